"""Verification: manufactured problems with exact solutions, a plastic impact with a known
answer, and the error norms of particle fields."""
