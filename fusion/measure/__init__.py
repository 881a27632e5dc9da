"""Crack measurement: length and width of a crack mask, in pixels or metres."""
