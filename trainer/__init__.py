"""PyTorch sidecar: datasets over shards and real folders, models, training, evaluation, prediction."""
