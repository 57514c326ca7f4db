"""Software-in-the-loop helicopter: hover model, LQI flight controller, ArduPilot-like MAVLink."""
