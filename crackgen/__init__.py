"""crackgen: synthetic RGB-D crack datasets from headless Blender, with simulated depth sensors."""
__version__ = "0.1.0"
