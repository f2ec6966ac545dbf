"""User tools run as `python -m tools.<name>`: the paper's tables, failure reports, checkpoint export, plots, results index."""
