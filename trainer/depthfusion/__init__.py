"""The stereo + ToF/LiDAR confidence CNN: model, data, augmentation, occluders, training, fusion and evaluation on renders and real scenes."""
