"""Runners: command-line programs that wire `coop_suite` and `agents`."""
