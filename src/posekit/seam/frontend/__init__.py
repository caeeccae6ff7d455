"""The front end: configuration, the robot program, simulated episodes, studies, the filterpy
peer, report and plots."""
