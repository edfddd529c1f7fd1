"""The participant kit: the submission format, intake checks, the in-sandbox agent runner and
example agents."""
