"""The application: command line, profiles, demo rig, runner, reports and plots."""
