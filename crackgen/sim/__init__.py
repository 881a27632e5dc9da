"""Geometry the sensors see: camera rig, mesh ray caster, ground truth and simulated depth sensors."""
