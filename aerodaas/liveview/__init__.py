"""Live-view helpers around the foxglove-sdk WebSocket server (:mod:`aerodaas.liveview.server`)."""
