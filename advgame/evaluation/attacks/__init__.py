"""Attacks learned ahead of a table: the searched optimal attack and exploitability."""
