"""`sdrpeer agent`: run one robot's agent as a process until SIGINT or SIGTERM.

How it works: `run_agent` sets up logging and runs `_serve`, which starts the `Agent`, waits for a
signal and stops it gracefully (leaving the cluster) within its preset's `stop_deadline`
(`sdrpeer.agent.timers`); past it, the agent SIGKILLs its component hosts and exits anyway,
logging what it was waiting for. A second SIGINT/SIGTERM does the same at once. The API answers
before the deployment stack has loaded; if it cannot load, the agent leaves and exits with 2.
SIGHUP re-reads the key file (`Agent.reload_keys`). Exit codes: 0 after a clean stop, 1 after a
forced or overdue one, 2 when the agent cannot start (configuration, address in use, key file).
"""

from __future__ import annotations

import asyncio
import logging
import signal

from sdrpeer.agent.agent import Agent
from sdrpeer.agent.logs import setup_logging
from sdrpeer.config import AgentConfig
from sdrpeer.errors import ConfigError

log = logging.getLogger("sdrpeer.agent")


async def _serve(config: AgentConfig) -> int:
    agent = Agent(config)
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    signals = 0
    main_task = asyncio.current_task()

    def on_signal() -> None:
        nonlocal signals
        signals += 1
        if signals == 1:
            log.info("shutting down (again to force)")
            stop.set()
        elif main_task is not None:
            agent.abort()  # no host outlives a forced exit
            main_task.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal)
    loop.add_signal_handler(signal.SIGHUP, agent.reload_keys)
    try:
        await agent.start(stack_in_background=True)  # the API answers while the rest loads
    except (ConfigError, OSError) as e:
        log.error("cannot start: %s", e)
        await agent.stop(leave=False)
        return 2
    failed: list[BaseException] = []

    def stack_done(task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            failed.append(task.exception())  # type: ignore[arg-type]
            stop.set()

    if agent.stack is not None:
        agent.stack.add_done_callback(stack_done)
    await stop.wait()
    if failed:
        log.error("cannot start the deployment stack: %r", failed[0])
        await _stop_within(agent, agent.tuning.agent.stop_deadline)
        return 2
    return await _stop_within(agent, agent.tuning.agent.stop_deadline)


async def _stop_within(agent: Agent, deadline: float) -> int:
    """A graceful stop bounded by `deadline` seconds; past it, say what hung and abort (exit 1)."""
    try:
        async with asyncio.timeout(deadline):
            await agent.stop()
    except TimeoutError:
        log.error(
            "stop still waiting for %s after %gs: killing the component hosts and exiting",
            agent.stopping,
            deadline,
        )
        agent.abort()
        return 1
    return 0


def run_agent(config: AgentConfig) -> int:
    """Run an agent until SIGINT/SIGTERM; returns the process exit code."""
    setup_logging(config.name, config.log_level, config.log_format)
    try:
        return asyncio.run(_serve(config))
    except asyncio.CancelledError:
        log.warning("forced exit")
        return 1
    except ConfigError as e:
        log.error("%s", e)
        return 2
