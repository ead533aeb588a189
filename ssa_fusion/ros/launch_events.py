"""What the launch files (launch_scripts/*.launch.py) share: arguments, self-shutdown.

Their launch arguments are declared alike (`launch_description`), and the graph shuts
itself down (`shutdown_handlers`).

`launch` is imported when called, not with this module: it is there under ``ros2 launch``
(and stood in for in tests), not in every environment that imports ssa_fusion.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping


def launch_description(arguments: Mapping[str, str], defaults: Mapping[str, str],
                       graph: Callable[[object], list[object]]) -> object:
    """Return a launch file's description: its launch arguments, then `graph` of their values.

    `arguments` maps each argument's name to its description, `defaults` to its default;
    `graph(context)` returns the nodes and event handlers of the values given (run by
    ``ros2 launch`` once they are known: an ``OpaqueFunction``).
    """
    # not installed here (no type information then either); there under `ros2 launch`
    from launch import LaunchDescription  # type: ignore[import-not-found, unused-ignore]
    from launch.actions import (  # type: ignore[import-not-found, unused-ignore]
        DeclareLaunchArgument,
        OpaqueFunction,
    )

    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=defaults[name], description=text)
          for name, text in arguments.items()),
        OpaqueFunction(function=graph),
    ])


def shutdown_handlers(sensor_sim: object, recorder: object, drain_s: float) -> list[object]:
    """Return two event handlers for a launch description (`launch` actions).

    When the `sensor_sim` action's process exits (its schedule is done), shut the launch
    down after `drain_s` wall s, in which the other nodes take what is still in flight; when
    the `recorder`'s exits (it died, or refused its parameters: a bag that exists already),
    at once, as nothing would be recorded and sensor_sim would wait for it forever.
    """
    # not installed here (no type information then either); there under `ros2 launch`
    from launch.actions import (  # type: ignore[import-not-found, unused-ignore]
        LogInfo,
        RegisterEventHandler,
        Shutdown,
        TimerAction,
    )
    from launch.event_handlers import OnProcessExit  # type: ignore[import-not-found, unused-ignore]

    done = OnProcessExit(target_action=sensor_sim, on_exit=[
        LogInfo(msg=f"sensor_sim exited: the rest of the graph stops in {drain_s:g} s"),
        TimerAction(period=drain_s, actions=[Shutdown(reason="sensor_sim finished")]),
    ])
    recorder_gone = OnProcessExit(target_action=recorder, on_exit=[
        Shutdown(reason="the recorder exited: nothing would be recorded"),
    ])
    return [RegisterEventHandler(done), RegisterEventHandler(recorder_gone)]
