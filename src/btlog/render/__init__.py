"""Rendering runs and trees for people: the terminal."""
