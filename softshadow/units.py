"""The paper's units of the two shadow parameters (Shoji, Murayama and Konno, Table 2).

Plain arithmetic, NumPy or Python numbers: reports and tables use it without loading JAX.
"""

__all__ = ["range_to_paper", "brightness_to_paper", "paper_to_range_k", "paper_to_rho"]


def range_to_paper(range_k):
    """Paper units of the range of the soft shadow: 100 k."""
    return 100.0 * range_k


def brightness_to_paper(rho):
    """Paper units of the brightness: 255 rho^(1/2.2) (lit = 255)."""
    return 255.0 * rho ** (1.0 / 2.2)


def paper_to_range_k(range_paper):
    return range_paper / 100.0


def paper_to_rho(brightness_paper):
    return (brightness_paper / 255.0) ** 2.2
