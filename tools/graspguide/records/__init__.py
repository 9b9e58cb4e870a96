"""The run records: what a run writes and every reader reads back. ``files``: the names of
a study folder and a session folder; ``trial``: the trial and TLX record types, their
fields and the readers' checks; ``frames``: a trial's frames file; ``storage``: the
crash-safe append and whole-file write, the JSON Lines reader and a session folder's
writer; ``events``: the events a run reports to its observers."""
