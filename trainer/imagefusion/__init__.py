"""Guided-filter fusion of exposure and focus stacks, as a command."""
