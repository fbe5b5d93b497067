"""Online identification while the robot works: an :class:`~wresdyn.adapt.adapter.Adapter` keeps an
offline calibration's physics up to date from the robot's stream of joint states and commands (:mod:`.adapter`,
settings in :mod:`.config`); :mod:`.stream` reads such a stream from a dataset or a text pipe, :mod:`.timeline`
writes and plots what the updates did."""
