"""Network model: device profiles, node map, configuration tracked from the log."""
