"""The calibrated robot leaves the project: USD layers Newton's importer reads, Newton actuators, the residual.

- :mod:`wresdyn.export.usd`: ``wresdyn export RUN`` writes ``robot.usda`` (a layer over the robot file with the
  identified physical parameters as the attributes Newton's USD importer reads) and ``actuated.usda`` (the drive
  path as ``newton.actuators`` prims: ``DrivePD``, ``Delay``, ``ClampingMaxEffort``; and the residual network).
- :mod:`wresdyn.export.convert`: an MJCF or URDF robot converted to USD first (``mujoco-usd-converter``,
  ``urdf-usd-converter``, run from their own ``.venv-usd``), the layers then written over the converted file.
- :mod:`wresdyn.export.servo_actuator`: the drive servo joints export to (dead band, goal profile, back-EMF) beside
  Newton's ``Delay`` and ``ClampingDCMotor``, registered with ``newton.actuators.register_actuator_component`` and a
  codeless USD schema; the export ships it as a self-contained file next to the layers.
- the residual network is written in the format every learner saves its networks in
  (:mod:`wresdyn.learn.network_file`: a ``torch.export`` archive and the same program as ONNX; loaded back with
  torch alone).
- :mod:`wresdyn.export.mjcf`: ``wresdyn export RUN --format mjcf`` writes ``robot.xml`` (the identified physics
  as MuJoCo's own joints and actuators, for any robot file) and the residual as ONNX;
  :mod:`wresdyn.export.play_mujoco` is the self-contained MuJoCo + onnxruntime loop shipped beside it.
- :mod:`wresdyn.export.residual_torque`: the small component a plain Newton script imports to run the exported
  residual every step (torch and warp only; it does not import the rest of wresdyn).
"""
