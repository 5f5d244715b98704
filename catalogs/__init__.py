"""Bundled bright-star catalog, sample TLE sets and loaders for user catalogs."""
