"""Driving Arena: shared configuration and the `arena` command line."""
