"""Training runs, checkpoints and predictions."""
