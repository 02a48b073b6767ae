"""Identification: from a rig's logged input and output to what a design needs.

- :mod:`~aiofl.identification.log`: the logged record (:class:`Log`) and its reader, which
  refuses a log that cannot identify anything (by column and row);
- :mod:`~aiofl.identification.excitation`: the input of an experiment (a PRBS or a chirp),
  as a CSV and a C array for a rig;
- :mod:`~aiofl.identification.records`: the JSON record of an identification;
- :mod:`~aiofl.identification.synthetic`: an independent scipy simulator that makes logs
  of a known plant (quantised, noisy, delayed), used by the tests and the benchmarks;
- the model-free route (ρ, b0, delay) and the grey-box route (a plant file's parameters).
"""
