"""Software in the loop: starting and stopping the processes of a simulated flight.

``processes``: one way to start a child (its own process group, a log file, optionally ending
with its parent), wait until it is ready and stop it with escalating signals, leaving nothing
behind; ``procfs``: what ``/proc`` says of a process and its descendants. ``vehicles``: the
command lines of ``sim-vehicle`` and ``companion run``, and the two started together on free
ports. ``companion demo``, ``companion fleet up``, the integration tests and the SITL
benchmarks start their processes with these. Nothing here imports ``sim_vehicle``: it is
started as a process (``python -m sim_vehicle.cli``).
"""
