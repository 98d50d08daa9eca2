"""The notch supervisor's collaborators, one job each (the facade is ``notch_supervisor``).

- :mod:`.config`: the settings (:class:`~.config.NotchConfig`, generated from
  ``parameter_specs``) and the settings in force shared by the collaborators;
- :mod:`.events`: what the supervisor did that the node logs or mirrors;
- :mod:`.sample_clock`: which loop sample it is at; gaps and duplicates counted;
- :mod:`.planning`: a set of changes checked as a whole, and what it leads to;
- :mod:`.plant_knowledge`: what the identifications found (G at the tones, G(f), lines);
- :mod:`.rate_policy`: coefficients, the bound on mu, its clamp, per-tone rates, prediction;
- :mod:`.gate`: whether control may run (held off with the reason) and since when it is on;
- :mod:`.fader`: the output's fade-out, after mu falls to 0 where asked;
- :mod:`.safety`: never worse than off (divergence guard, line offset, anti-windup count);
- :mod:`.identification`: the plant's identification from its start to control on;
- :mod:`.tone_follower` over :mod:`.reference_input`, :mod:`.acquisition`,
  :mod:`.phase_detector`, :mod:`.retuning` and :mod:`.sweep_gate`: moving tones.
"""
