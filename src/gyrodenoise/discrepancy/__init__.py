"""Discrepancy workflow: compare simulated and measured gyros, name the missing effects."""
