"""What every part of the trainer shares: errors, checkpoints, image I/O, the device rule, seeded hold-outs."""
