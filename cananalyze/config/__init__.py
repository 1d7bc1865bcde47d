"""The network/rules configuration file (one schema), its line-numbered errors, and the configuration timeline each node follows."""
