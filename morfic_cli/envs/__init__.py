"""The locomotion environment (rsl-rl ``VecEnv``): observations, rewards, commands, terminations, DR."""
