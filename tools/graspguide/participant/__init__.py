"""The virtual participant: a seeded model of a person following the vibrotactile cues.
Everything it produces is simulated and labelled so."""
