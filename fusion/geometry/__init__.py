"""Camera model, projection and z-buffer, disparity, lens distortion, SGBM stereo and real-scene loaders: the geometry every other part shares."""
