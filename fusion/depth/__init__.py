"""Depth fusion: dense candidate maps, the confidence rules, post-filters, the CNN's inputs, disparity metrics and scan-line LiDAR."""
