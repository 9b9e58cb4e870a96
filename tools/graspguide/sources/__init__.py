"""Where poses come from: synthetic and recorded poses, lab trackers (LSL, NatNet), and
the per-trial source a run opens (the virtual participant or an open loop)."""
