"""Coder examples (scripts to run, not modules to import)."""
