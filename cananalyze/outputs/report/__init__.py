"""The HTML report: accumulators, plots, sections and the page, one sink."""
