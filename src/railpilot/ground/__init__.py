"""The ground dispatch application of paper 001: no I/O, time passed in (like the link core).

Train registry and live state, timetable, block occupancy and target points, online
running-time re-optimisation, TSR management. The transports (net/, web/) feed
it; the store keeps what must survive a restart.
"""
