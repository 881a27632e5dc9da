"""Running the data path: per-sample pipeline, shard tasks, local and Ray back ends, the generate driver."""
