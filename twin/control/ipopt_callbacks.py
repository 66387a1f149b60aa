"""The coarse shooting OCP as CasADi callbacks, so IPOPT sees its cost, exact gradient and Hessian.

IPOPT (through ``casadi.nlpsol``) asks for f(p), grad f(p) and a Hessian of the Lagrangian;
:func:`casadi_objective` wraps :class:`twin.control.shooting.CoarseShooting` (one forward sweep
serves all three, cached per p) in ``casadi.Callback`` objects that the feedforward passes as
the options ``grad_f`` and ``hess_lag`` (stack-notes.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from twin.control.shooting import CoarseShooting


def casadi_objective(shooting: CoarseShooting, n_g: int) -> tuple[Any, Any, Any]:
    """(f, grad_f, hess_lag) CasADi Callbacks for ``nlpsol`` (options "grad_f", "hess_lag").

    The Hessian of the Lagrangian is the Gauss-Newton matrix of the cost times lam_f
    (the constraints of the OCP are linear and add nothing).
    """
    import casadi as ca

    npar = shooting.map.n_params
    dense = ca.Sparsity.dense(npar, 1)

    class _Jac(ca.Callback):
        def __init__(self, name: str, opts: dict[str, Any]) -> None:
            ca.Callback.__init__(self)
            self.construct(name, opts)

        def get_n_in(self) -> int:
            return 2

        def get_n_out(self) -> int:
            return 1

        def get_sparsity_in(self, i: int) -> Any:
            return dense if i == 0 else ca.Sparsity.dense(1, 1)

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(1, npar)

        def eval(self, arg: Any) -> Any:
            g = shooting.sweep(np.asarray(arg[0], float).ravel()).grad
            assert g is not None
            return [ca.DM(g).T]

    class _Objective(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self._jac: Any = None
            self.construct("ocp_cost", {})

        def get_n_in(self) -> int:
            return 1

        def get_n_out(self) -> int:
            return 1

        def get_sparsity_in(self, i: int) -> Any:
            return dense

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(1, 1)

        def eval(self, arg: Any) -> Any:
            return [shooting.cost(np.asarray(arg[0], float).ravel())]

        def has_jacobian(self) -> bool:
            return True

        def get_jacobian(self, name: Any, inames: Any, onames: Any, opts: Any) -> Any:
            self._jac = _Jac(name, opts)
            return self._jac

    class _Grad(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("ocp_grad_f", {})

        def get_n_in(self) -> int:
            return 2

        def get_n_out(self) -> int:
            return 2

        def get_name_in(self, i: int) -> str:
            return ["x", "p"][i]

        def get_name_out(self, i: int) -> str:
            return ["f", "grad"][i]

        def get_sparsity_in(self, i: int) -> Any:
            return dense if i == 0 else ca.Sparsity(0, 0)

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(1, 1) if i == 0 else dense

        def eval(self, arg: Any) -> Any:
            r = shooting.sweep(np.asarray(arg[0], float).ravel())
            assert r.grad is not None
            return [r.cost, ca.DM(r.grad)]

    class _Hess(ca.Callback):
        def __init__(self, n_g: int) -> None:
            ca.Callback.__init__(self)
            self.n_g = n_g
            self.construct("ocp_hess_lag", {})

        def get_n_in(self) -> int:
            return 4

        def get_n_out(self) -> int:
            return 1

        def get_name_in(self, i: int) -> str:
            return ["x", "p", "lam_f", "lam_g"][i]

        def get_name_out(self, i: int) -> str:
            return "hess"

        def get_sparsity_in(self, i: int) -> Any:
            return [dense, ca.Sparsity(0, 0), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(self.n_g, 1)][i]

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.upper(npar)

        def eval(self, arg: Any) -> Any:
            r = shooting.sweep(np.asarray(arg[0], float).ravel())
            assert r.hess is not None
            lam_f = float(arg[2])
            return [ca.triu(ca.DM(lam_f * r.hess))]

    return _Objective(), _Grad(), _Hess(n_g)


def stop_when(stopped: Callable[[], bool], n_x: int, n_g: int) -> Any:
    """An ``iteration_callback`` for ``nlpsol`` that ends IPOPT ("User_Requested_Stop") once ``stopped()`` is true.

    The budget's check raises in the cost callbacks, but IPOPT takes a failed evaluation for a bad trial point: it
    cuts its step and restores, about 22,000 failed evaluations (a minute) before it gives up, and CasADi's
    ``eval_errors_fatal`` is not acted on by its IPOPT interface (3.8).  IPOPT asks this callback at every
    iteration, restoration included, so a cancel ends the solve within one iteration.
    """
    import casadi as ca

    class _Stop(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("ocp_stop", {})

        def get_n_in(self) -> int:
            return int(ca.nlpsol_n_out())

        def get_n_out(self) -> int:
            return 1

        def get_name_in(self, i: int) -> str:
            return str(ca.nlpsol_out(i))

        def get_sparsity_in(self, i: int) -> Any:
            size = {"x": n_x, "f": 1, "g": n_g, "lam_x": n_x, "lam_g": n_g, "lam_p": 0}[str(ca.nlpsol_out(i))]
            return ca.Sparsity.dense(size, 1)

        def eval(self, arg: Any) -> Any:
            return [1.0 if stopped() else 0.0]

    return _Stop()
