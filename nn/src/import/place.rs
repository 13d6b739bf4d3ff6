//! Reading and setting a burn module's parameters by path (`enc.0.res.norm1.gamma`), the
//! names the import tables map official keys to.

use std::collections::BTreeMap;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Tensor, TensorData};

/// Every float parameter's path and shape.
pub fn shapes<M: Module>(module: &M) -> BTreeMap<String, Vec<usize>> {
    let mut v = Shapes { path: Vec::new(), out: BTreeMap::new() };
    module.visit(&mut v);
    v.out
}

struct Shapes {
    path: Vec<String>,
    out: BTreeMap<String, Vec<usize>>,
}

impl ModuleVisitor for Shapes {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.out.insert(self.path.join("."), param.val().dims().to_vec());
    }
}

/// A PyTorch Linear weight (`[out, in]`, row-major) in burn's layout (`[in, out]`).
pub fn transpose(w: &[f32], din: usize, dout: usize) -> Vec<f32> {
    (0..din * dout).map(|n| w[(n % dout) * din + n / dout]).collect()
}

/// Sets `module`'s float parameters from `values` by path. Returns the module and the paths
/// of its parameters `values` had nothing for; `values` keeps what matched no parameter.
/// The caller has checked the shapes ([`shapes`]).
pub fn place<M: Module>(module: M, values: &mut BTreeMap<String, TensorData>) -> (M, Vec<String>) {
    let mut m = Place { path: Vec::new(), values: std::mem::take(values), unset: Vec::new() };
    let module = module.map(&mut m);
    *values = m.values;
    (module, m.unset)
}

/// [`place`] every value into `module`, for the importer of `path`: a parameter left unset or a
/// value matching no parameter is [`ImportError::Apply`] (a mapping bug, not a bad file).
///
/// # Errors
/// [`ImportError::Apply`] naming the unset parameters and the unused values.
pub fn place_all<M: Module>(
    module: M,
    mut values: BTreeMap<String, TensorData>,
    path: &std::path::Path,
) -> Result<M, super::ImportError> {
    let (module, unset) = place(module, &mut values);
    if unset.is_empty() && values.is_empty() {
        return Ok(module);
    }
    let unused: Vec<&String> = values.keys().collect();
    Err(super::ImportError::Apply {
        path: path.into(),
        what: format!("parameters left unset {unset:?}, values unused {unused:?}"),
    })
}

struct Place {
    path: Vec<String>,
    values: BTreeMap<String, TensorData>,
    unset: Vec<String>,
}

impl ModuleMapper for Place {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let path = self.path.join(".");
        match self.values.remove(&path) {
            Some(data) => param.map(|t| Tensor::from_data(data, &t.device())),
            None => {
                self.unset.push(path);
                param
            }
        }
    }
}
