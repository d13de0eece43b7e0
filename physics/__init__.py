"""Physics of ionic electroactive-polymer actuators (IPMC, IP2C): device parameters,
switchable physical effects, frequency- and time-domain solvers, signals, measurements."""
