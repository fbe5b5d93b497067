"""Grey-box identification of the simulator's own physics (gains, armature, damping, friction, effort limits, delay,
link masses) from the recordings: :mod:`.sysid` (the fit, its settings in :mod:`.sysid_config`, multiple shooting from
:mod:`.shooting`, a coarse start from :mod:`.grid_search`), :mod:`.unexcited_limits` (effort limits the recordings
never reach) and :mod:`.identifiability` (how well the data pin each parameter down)."""
