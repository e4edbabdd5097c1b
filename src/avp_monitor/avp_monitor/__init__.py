"""The episode monitor (:mod:`.monitor`) and the closed-loop step time it measures (:mod:`.step_timer`)."""
