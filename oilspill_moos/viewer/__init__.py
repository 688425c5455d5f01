"""pMarineViewer: the oil-spill operations map in a browser (model, page server, MOOS app, replay)."""
