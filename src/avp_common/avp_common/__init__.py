"""ROS glue shared by the AVP nodes: message <-> core conversions, QoS profiles, validated parameters."""
