"""The device settings an operator may give a run (``hilbench run --OPTION``, the GUI's device settings and a
campaign's ``[settings]``): name -> (unit, what it sets). One table, read by the CLI and the GUI alike."""

DEVICE_OPTIONS = {
    "current_limit": ("A", "device current limit"),
    "velocity_limit": ("rad/s", "device velocity limit"),
    "position_min": ("rad", "lower end of the position window"),
    "position_max": ("rad", "upper end of the position window"),
    "watchdog_timeout": ("s", "device watchdog timeout (0 = off)"),
    "torque_constant": ("N*m/A", "calibration: torque constant"),
    "counts_per_rev": ("counts", "calibration: encoder counts per motor revolution"),
    "ratio": ("1", "calibration: motor revolutions per load revolution"),
    "position_kp": ("A/rad", "position loop: proportional gain (position mode)"),
    "position_ki": ("A/(rad*s)", "position loop: integral gain (0 = off)"),
    "position_kd": ("A*s/rad", "position loop: derivative gain (0 = off)"),
    "position_i_limit": ("A", "position loop: bound of the integral term"),
    "position_d_cutoff": ("Hz", "position loop: low-pass of the derivative (0 = unfiltered)"),
}
