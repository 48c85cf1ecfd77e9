"""Pictures of runs (extra ``mmrl[viz]``): videos and stills (``render``, with its small
``camera``) and learning-curve and trajectory plots (``plots``). The browser viewer is
:mod:`mmrl.viewer`."""
