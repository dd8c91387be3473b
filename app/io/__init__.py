"""Results on disk: history, summary, ParaView fields, plots."""
