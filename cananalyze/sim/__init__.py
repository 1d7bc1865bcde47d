"""Device simulator for samples and live tests."""
