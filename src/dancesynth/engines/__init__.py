"""Synthesis engines. Each turns MusicFeatures (+ a motion database) into motion."""
