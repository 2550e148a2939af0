//! The paper's reduced models and preview controllers.
