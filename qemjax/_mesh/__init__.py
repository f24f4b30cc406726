"""Mesh data, connectivity and geometric queries (numpy, no JAX)."""
