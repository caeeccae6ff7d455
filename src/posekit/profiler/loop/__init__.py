"""The closed loop of the paper's §IV-C: robot and sensor simulators, the PD compensation,
step-response metrics, the Table III/IV experiment over loopback sockets and its report, and
the OpenCV camera pipeline that Table III compares against."""
