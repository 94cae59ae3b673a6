#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod descriptor;
pub mod dynamic;
pub mod error;
pub mod message;
pub mod roles;
pub mod schedule;
pub mod settings;
pub mod wire;

pub use descriptor::{BaseType, FieldDescriptor, FieldType, MessageDescriptor, MessageSet};
pub use error::{DecodeError, EncodeError};
pub use message::{Decode, Message, priority};
pub use wire::{Chars, VarArray};
