"""SMARTS agent specs, as the zoo names them."""
