"""Offline training of the learned trajectory predictor (docs/trajectory_model.md): its data from simulated episodes
(:mod:`.data`), training and evaluation (:mod:`.train`) and the `avp train-trajectory` command (:mod:`.run`). It
shares the intent CNN's data generation in avp_training; the runtime packages never import it."""
