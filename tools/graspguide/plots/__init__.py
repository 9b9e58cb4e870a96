"""`graspguide plot`: pictures of trials. ``run_folder`` reads a study folder (`graspguide
trial`) or a session folder (`graspguide stream --log`); ``figures`` draws a trial (error
angle with the threshold and the hold window, PWM per finger) and a participant's session
overview; ``structure`` describes a figure as JSON (what the tests compare instead of
pixels); ``command`` writes the PNG and SVG files. matplotlib is imported only when a
figure is drawn, so registering the subcommand costs nothing at start-up."""
