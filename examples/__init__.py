"""Worked examples of extending coop-suite (docs/extending.md)."""
