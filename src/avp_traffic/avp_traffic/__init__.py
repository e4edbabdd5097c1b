"""ROS-free traffic: a lot's lane graph (:mod:`.lanes`), seeded traffic of cars that enter, search, park and leave
(:mod:`.traffic`, :mod:`.agents`, :mod:`.types`), the busy-lot scenario family (:mod:`.busy`) and the rule by which
agents yield to an ego (:mod:`.agent_yield`)."""
