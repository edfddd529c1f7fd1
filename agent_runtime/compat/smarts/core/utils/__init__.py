"""SMARTS utilities agents import."""
