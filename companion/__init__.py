"""Companion service: GART/M-GART planning, G1/G2 smoothing, threat management, MAVLink link."""

__version__ = "0.1.0"
