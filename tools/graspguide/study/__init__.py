"""Running a study: the trial runner, the stream session, the pose loop, the demo, the
dry run, the operator console and the live view, and the job pool they share."""
