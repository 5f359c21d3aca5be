"""Review effort: what a careful annotator does with proposals, knowing the truth, and the time it takes a person.

Pure of the backend: `plan` decides per proposal, `costs` prices the actions, `session` works a queue of
proposals (the backend's over HTTP in `app.simulation`, or one in memory here) and `review_time` scores a
proposer by it, which the VMA retrain job uses as its second gate.
"""
