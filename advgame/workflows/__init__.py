"""Workflows built on the library: campaigns, the zoo, PSRO, ready-made evaluations, the demo."""
