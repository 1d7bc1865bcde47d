"""The CANopen rules and the rules file's assertions, one rule per module."""
