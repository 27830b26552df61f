"""Human studies: studies, their frames, participants, trials, clicks and events."""
