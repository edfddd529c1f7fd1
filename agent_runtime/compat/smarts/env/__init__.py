"""SMARTS environments: only the wrappers of the competition kit here."""
