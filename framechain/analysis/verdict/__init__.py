"""From fits to a verdict: attribution, findings and their fixes, the bounds of what the evidence could see, the
curves to check by eye, corrections applied to a log, and what a finding means on this episode."""
