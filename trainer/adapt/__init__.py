"""Adapting a trained model to a site's unlabeled photos after training: AdaBN checkpoints and pseudo-labels."""
