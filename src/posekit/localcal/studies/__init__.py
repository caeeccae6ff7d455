"""The studies part of localcal: experiments that run the methods on the simulator.

:mod:`.episode`
    One look-then-move episode (:func:`~.episode.run_localcal_episode`): the simulator's arm,
    camera and VO, and the methods and registration on what they measure.
:mod:`.episode_config`
    The episode's settings (:class:`~.episode_config.EpisodeConfig`) and their vocabularies.
:mod:`.experiments`
    Repeated episodes and the paper's Tables 2–4 (``posekit localcal simulate`` and ``demo``).
:mod:`.simulate`
    ``posekit localcal simulate`` and ``demo`` as library calls (:func:`~.simulate.simulate`,
    :func:`~.simulate.demo`) and the episode settings of their options.
:mod:`.plots`
    The figures (Figs. 5–9), tables as text and CSV, ``results.json`` and ``report.html``
    (matplotlib imported only when drawing).

Studies may import every other part; nothing outside the studies and the CLI imports them.
"""

__all__ = ["episode", "episode_config", "experiments", "plots", "simulate"]
