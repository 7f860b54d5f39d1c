"""The simulated devices: real protocol peers (the hilbench amplifier on a pty or CAN, a CiA 402 drive, an ODrive)
that run the engine's plant in their own process. They share only protocol definitions with drivers."""
