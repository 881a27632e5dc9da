"""Sensor geometry and classical fusion: pure numpy/OpenCV, shared by generator and trainer."""
