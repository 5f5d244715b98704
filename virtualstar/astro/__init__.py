"""Astronomy: from a target, a site and a time to where the mount must point."""
