"""Firmware of the ankle-foot prosthesis: runs against hal interfaces only."""
