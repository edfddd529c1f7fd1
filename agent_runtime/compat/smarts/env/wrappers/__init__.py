"""The competition kit's environment wrappers."""
