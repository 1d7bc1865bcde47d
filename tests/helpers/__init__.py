"""Test helpers: small third-party-facing fixtures (a CiA 301 SDO block server)."""
