"""Vehicle controllers used in closed-loop simulation (paper 000's LQR line tracker)."""
