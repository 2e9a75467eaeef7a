"""ROS 2 plumbing shared by every node of the catheter graph.

The device drivers (``catheter_driver``) and the controller side (``catheter_control``) both
build on this package and never on each other: they meet only at the topic contract
(``catheter_models.contract``). Nothing here knows a device or a model.

- ``node_main``: a node's process entry (signals, executor, exit codes, ``--ros-args``).
- ``rt_loop`` and ``loop_node``: the deadline loop thread and a node that owns one.
- ``params``: strict, typed, range-checked parameters.
- ``qos``: the contract's QoS profiles and REP 2003 overridable publishers.
- ``lifecycle_node`` and ``lifecycle_client``: the managed-node side and the manager side.
- ``polled``: subscriptions a loop reads without the executor.
- ``diagnostics`` and ``messages``: ``/diagnostics`` status and message conversion.
"""
