"""Scenario definitions, map templates, generators and the hidden/public suites."""
