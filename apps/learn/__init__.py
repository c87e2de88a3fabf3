"""The learning environments on asset2sim's outputs: :mod:`.task` (which joint a task text moves, from where to
where), :mod:`.gym_env` (a Gymnasium environment per task, the learnability benchmark's; extra ``gym``),
:mod:`.mjx_env` (an MJX environment for brax's PPO, a CPU's few or a GPU's thousands; extra ``learn-mjx``) and
:mod:`.maniskill` (ManiSkill 3 environments, ``import asset2sim.apps.learn.maniskill`` registers them; extra
``maniskill``). Importing the package imports none of them."""
