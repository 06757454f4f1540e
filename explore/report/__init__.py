"""What happened: figures and summaries of runs and campaigns, and the rerun recording of an
exploration (recorder and viewer layout)."""
