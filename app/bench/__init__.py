"""Measurements of cost and endurance, kept apart from the product: `headway bench` (pipeline.py, with
particles.py), and the scripts run as `python -m app.bench.NAME`: phd (the phd tracker against the vehicles
it holds), can_output (sending Headway's CAN frames), fleet (drives per minute on Dask) and soak (the service
for an hour on a looping clip). They sit above everything they measure in the layer order
(tests/test_layers.py); only the CLI and `headway eval`'s cost part import them."""
