"""Lab tools for training campaigns, above the trainer: learning curves (``curves``), A/B window
means of branched runs (``compare``) and curriculum levels per terrain type from a checkpoint
(``levels``). ``foottof.eval`` may use them; the trainer (``foottof.ppo``) does not."""
