"""What a study asks: the study-protocol and scene files, and the NASA-TLX questionnaire."""
