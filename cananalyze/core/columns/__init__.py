"""Column builders: text, hex, numbers, JSON and Arrow arrays from numpy
columns, without a Python object per row."""
