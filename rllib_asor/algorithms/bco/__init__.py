"""BCO (Torabi, Warnell, Stone, IJCAI 2018, "Behavioral Cloning from Observation") on RLlib's new
API stack: an inverse dynamics model p(a | s, s′) learnt from the agent's own transitions infers
the expert's actions from state-only demonstrations; the policy is cloned on them.

Online, BCO(α): the first iteration samples `pre_demo_steps` with random actions (the paper's
pre-demonstration phase), every later one α·`pre_demo_steps` more with the policy; each
iteration the model learns from all of them, relabels the expert transitions and the policy is
cloned on the new labels. Offline (`input_` set): no interaction; the model learns from the
dataset's own transitions and actions.

- `settings.py`: `BcoSettings`, the YAML `bco:` block;
- `learner.py`: the Learner (behavioural cloning's loss on the inferred actions);
- `config.py`: `BcoConfig` / `BCO` (the loop above, the model on the driver).
"""
