"""Evidence at scale: a suite of episodes (:mod:`.suite`), run locally or on Dask and
resumable (:mod:`.run`), summarised with intervals and paired comparisons (:mod:`.stats`,
:mod:`.report`). docs/evaluation.md."""
