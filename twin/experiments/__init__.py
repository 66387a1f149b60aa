"""What a user runs with the closed loop, and what is written about it: a headless run (``run``), the
paper's campaign (``campaign``), an open-loop simulation (``simulate``), their figures, the one-page report
and the model error against the truth."""
