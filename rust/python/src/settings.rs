//! Frozen settings classes without a constructor to keep in step with their fields: the
//! fields are listed once, and the class is built by keyword or position from them.

/// A frozen settings class. `Name(core::Struct) { field: Type, ... }` wraps a core struct of
/// those fields; `Name { field: Type, ... }` is a struct of its own. Its repr shows the fields.
macro_rules! settings_class {
    ($(#[$doc:meta])* $name:ident($($core:ident)::+) { $($field:ident: $ty:ty),+ $(,)? }) => {
        $(#[$doc])*
        #[pyclass(module = "aptkt._core", frozen)]
        pub struct $name(pub $($core)::+);

        #[pymethods]
        impl $name {
            #[new]
            fn new($($field: $ty),+) -> Self {
                Self($($core)::+ { $($field),+ })
            }

            fn __repr__(&self) -> String {
                format!("{:?}", self.0)
            }
        }
    };
    ($(#[$doc:meta])* $name:ident { $($(#[$fdoc:meta])* $field:ident: $ty:ty),+ $(,)? }) => {
        $(#[$doc])*
        #[pyclass(module = "aptkt._core", frozen)]
        #[derive(Clone, Debug)]
        pub struct $name {
            $($(#[$fdoc])* pub $field: $ty),+
        }

        #[pymethods]
        impl $name {
            #[new]
            fn new($($field: $ty),+) -> Self {
                Self { $($field),+ }
            }

            fn __repr__(&self) -> String {
                format!("{self:?}")
            }
        }
    };
}
pub(crate) use settings_class;
