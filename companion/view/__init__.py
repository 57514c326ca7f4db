"""The operator's view: the flight as Foxglove channels (MCAP file and live WebSocket server).

- :mod:`companion.view.scene`: pure builders of the 3D scene (NED -> ENU, tubes, shapes);
- :mod:`companion.view.channels`: topics and the JSON schemas of the companion's messages;
- :mod:`companion.view.publisher`: ``FlightView``, the record interface onto both sinks;
- :mod:`companion.view.mcap_record`: an MCAP flight read back for ``companion report``.
"""
