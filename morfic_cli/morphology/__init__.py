"""Robot library, the 11-D morphology descriptor, and the MJCF builder."""
