"""The threat decision (DESIGN 7, paper section 3.3), pure: threats to space-time tubes
(``prediction``), the one check (``spacetime``), the escape library (``evasion``), time warps of
the active path (``retime``), the one splice (``join``), M-GART switching targets
(``alternatives``), each strategy's candidates (``candidates``), the cost and the outcome
(``choice``), the words as enums (``kinds``) and the decision as a pure step
``decide(state, observation) -> (decision, state)`` (``step``). No asyncio, no zenoh, no clock
of its own."""
