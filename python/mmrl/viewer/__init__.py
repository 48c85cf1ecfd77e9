"""The browser viewer (``mmrl view``, ``mmrl play``, ``mmrl render --html``; extra ``mmrl[viewer]``).

- :mod:`.scene`: the one module that calls viser;
- :mod:`.draw`: what a frame shows (the figure, target, obstacles, sensors, trajectories, contacts);
- :mod:`.clips`: playbacks of a run, a BVH file or a database;
- :mod:`.view_app`: ``mmrl view``; :mod:`.export`: ``mmrl render --html``;
- :mod:`.live`: ``mmrl play``'s loop, headless (testable without a browser);
  :mod:`.play_app`: its controls on the Scene.
"""
