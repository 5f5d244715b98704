"""TPOINT-style pointing model for alt-azimuth mounts: terms, fit, apply and invert."""
