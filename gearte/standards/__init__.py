"""Gear accuracy standards (ISO 1328)."""
