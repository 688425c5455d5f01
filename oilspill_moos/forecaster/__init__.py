"""LTC spill-boundary forecaster: data, features, models, training, evaluation and the TCP push."""
