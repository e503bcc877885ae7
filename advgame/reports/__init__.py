"""Writing results: Markdown reports and PNG figures of payoff tables, runs and campaigns."""
