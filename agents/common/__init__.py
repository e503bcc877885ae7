"""The common room: what every learner family shares.

Replay storage (`replay_store`), observation normalizers (`normalizer`), the numpy forward of
saved SB3 actors (`forward`, `sb3_policy`, `recurrent_policy`), checkpoints as policy specs
(`checkpoint`), episode statistics (`stats`) and a training side (`side`). It imports advgame's
core only, never a family.
"""
