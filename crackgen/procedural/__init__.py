"""Procedural content in surface coordinates: noise, crack map, surface mesh, PBR maps, distractors, shadow masks."""
