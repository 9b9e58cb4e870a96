"""Host tools for the MicroPython port (micropython/): the plan file a board reads
(:mod:`.plan_file`), the staged build and its copy to a board with mpremote
(:mod:`.deploy`), and starting it there (:mod:`.run`)."""
