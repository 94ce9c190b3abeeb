"""Random and recorded loads: stationary statistics, Monte Carlo with friction, record
histories, their designs."""
