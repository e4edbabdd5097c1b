"""Prediction of the other cars (paper §V-B, §V-C): which spot each will take, and how it gets there.

:mod:`.intention` (the intentions of one agent), :mod:`.intent_net`, :mod:`.intent_features` and :mod:`.intent_model`
(the intent CNN on the BEV; shipped weights in ``models/``), :mod:`.implicit` (the implicit baseline),
:mod:`.prediction` (the predictor interface, Bézier and constant velocity), :mod:`.prediction_astar` (Hybrid A*
predictions), :mod:`.learned_prediction` and :mod:`.trajectory_net` (the learned trajectory transformer). Nothing here
imports rclpy; avp_perception's pipeline and nodes sit on top.
"""
