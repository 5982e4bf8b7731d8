//! probegi-bevy's tests, one binary (Bevy's test binaries are large to link).

mod examples;
mod extract;
mod field_lighting;
mod field_on_bevy_device;
mod sky_on_device;
