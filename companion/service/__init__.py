"""The parts of ``companion.daemon``, one job each: background tasks, the mission, the legs,
the summary. ``CompanionDaemon`` (``companion.daemon``) puts them together."""
