"""Starting the rig's nodes as processes, the way ``ros2 run`` / ``ros2 launch`` start them (:mod:`.rosrun`), and the
whole simulated rig with its observer and run summary (:mod:`.rig`): used by ``crane-stiffness campaign run``, the
demo, the tests and the benchmarks."""
