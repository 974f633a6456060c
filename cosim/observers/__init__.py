"""Observers of a run: recorders and tracking statistics, the MCAP log and its writer process, the channels both
the log and the live view publish, the live view, real-time pacing. They watch; they never change inputs."""
