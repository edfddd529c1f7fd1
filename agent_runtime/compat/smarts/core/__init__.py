"""SMARTS core types an agent reads."""
