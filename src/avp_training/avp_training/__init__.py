"""Training of the intent CNN of §V-A on simulated traffic (ROS-free; model card: docs/intent_model.md).

* :mod:`.lots` — training lots: the DLP-derived lot (``maps/dlp_west.yaml``) and seeded random grid lots;
  the paper's experiment lot is kept for testing;
* :mod:`.lanes` — lane graph of a lot, exact straight/arc paths and a tracker that drives them with eq. (1);
* :mod:`.traffic` — seeded traffic as VehicleAgent plans: cars that enter, explore, pick a spot by a
  stochastic rule and park with one of ParkSim's 8 maneuvers, cars that leave, and the observer's tour;
* :mod:`.dataset` — samples exactly as the live pipeline sees them (World observation -> eq. (7) ->
  :meth:`IntentPredictor.inputs`), labels, compact storage, splits by seed;
* :mod:`.train` — grouped loss, training with early stopping on a validation split, evaluation and the
  nearest-spot baselines;
* :mod:`.run` — ``avp train-intent`` / ``avp gen-intent-data``.
"""
