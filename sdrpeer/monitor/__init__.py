"""Monitoring: metric sources (real and virtual), scenarios, link estimators and traps."""
