"""The agent side of components: instance specs, supervisors, reconciling.

How it works: the desired set of instances (`spec.InstanceSpec`, set through the API or, later, the
allocator's plans) goes to the `manager.InstanceManager`. Its loop asks the pure
`reconciler.Reconciler` what to do given what each `supervisor.Supervisor` observes, and carries the
actions out: a supervisor starts its host process, talks to it over a
`sdrpeer.control.agent_side.ControlChannel` (docs/protocol.md) and restarts it with backoff
(`backoff.RestartPolicy`) when it dies.
"""
