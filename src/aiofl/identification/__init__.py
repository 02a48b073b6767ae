"""Identification: from a rig's logged input and output to what a design needs.

- :mod:`~aiofl.identification.log`: the logged record (:class:`Log`) and its reader, which
  refuses a log that cannot identify anything (by column and row);
- :mod:`~aiofl.identification.excitation`: the input of an experiment (a PRBS or a chirp),
  as a CSV and a C array for a rig;
- :mod:`~aiofl.identification.records`: the JSON record of an identification;
- :mod:`~aiofl.identification.synthetic`: an independent scipy simulator that makes logs
  of a known plant (quantised, noisy, delayed), used by the tests and the benchmarks;
- the model-free route, what an ADRC design needs from the log alone:
  :mod:`~aiofl.identification.chain_fit` (an output-error fit of a chain plus delay),
  :mod:`~aiofl.identification.chain` (ρ by BIC, b0 with its standard error, the delay),
  :mod:`~aiofl.identification.offline_eso` (the ESO run over the log: is the total
  disturbance small and smooth?), :mod:`~aiofl.identification.first_config` (a first LADRC
  config and its chain plant file);
- the grey-box route, a plant's parameters: :mod:`~aiofl.identification.grey_box` (a
  batched global search, then least squares on the simulation error, with standard errors),
  :mod:`~aiofl.identification.output_injection` (closed-loop logs of unstable plants),
  :mod:`~aiofl.identification.residuals` (whiteness and independence tests),
  :mod:`~aiofl.identification.fitted_plant` (the fitted plant file and the
  ``[uncertainty]`` box).
"""
