"""The flight record: written as the flight goes (``flight_record``), read back and drawn
(``report``, ``report_scene``). MCAP records are read by ``companion.view.mcap_record``."""
