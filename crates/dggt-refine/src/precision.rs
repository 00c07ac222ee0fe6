//! The float types the refiner's two networks compute in.
//!
//! The UNet and the VAE are cast separately: sd-turbo's VAE configuration asks for f32 (`force_upcast`:
//! its decoder's activations can leave f16's range on large images), so the common reduced-precision choice is
//! the UNet alone ([`RefinerPrecision::unet_only`]); both reduced ([`RefinerPrecision::all`]) halves the
//! VAE's memory too. Whatever the choice, images, latents, the scheduler's step and the result are f32: each
//! network casts its input to its own type and its output back.

use burn::tensor::FloatDType;

use crate::error::UnknownName;

/// The UNet's and the VAE's float types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RefinerPrecision {
    pub unet: FloatDType,
    pub vae: FloatDType,
}

impl Default for RefinerPrecision {
    fn default() -> Self {
        Self::all(FloatDType::F32)
    }
}

impl RefinerPrecision {
    /// Both networks in `dtype`.
    pub fn all(dtype: FloatDType) -> Self {
        Self { unet: dtype, vae: dtype }
    }

    /// The UNet in `dtype`, the VAE in f32.
    pub fn unet_only(dtype: FloatDType) -> Self {
        Self { unet: dtype, vae: FloatDType::F32 }
    }

    /// The name on command lines: `f32`, `f16`, `bf16` (both networks) or `f16-unet`, `bf16-unet` (the UNet
    /// alone).
    pub fn name(self) -> String {
        let name = |dtype: FloatDType| match dtype {
            FloatDType::F16 => "f16".to_string(),
            FloatDType::BF16 => "bf16".to_string(),
            FloatDType::F32 => "f32".to_string(),
            other => format!("{other:?}").to_lowercase(),
        };
        match (self.unet, self.vae) {
            (unet, vae) if unet == vae => name(unet),
            (unet, FloatDType::F32) => format!("{}-unet", name(unet)),
            (unet, vae) => format!("unet {}, vae {}", name(unet), name(vae)),
        }
    }
}

impl std::str::FromStr for RefinerPrecision {
    type Err = UnknownName;

    fn from_str(text: &str) -> Result<Self, UnknownName> {
        let dtype = |name: &str| match name {
            "f32" => Some(FloatDType::F32),
            "f16" => Some(FloatDType::F16),
            "bf16" => Some(FloatDType::BF16),
            _ => None,
        };
        let parsed = match text.strip_suffix("-unet") {
            Some(unet) => dtype(unet).map(Self::unet_only),
            None => dtype(text).map(Self::all),
        };
        parsed.ok_or_else(|| UnknownName {
            what: "refiner precision",
            text: text.to_string(),
            expected: "f32, f16, bf16, f16-unet or bf16-unet",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back() {
        for name in ["f32", "f16", "bf16", "f16-unet", "bf16-unet"] {
            assert_eq!(name.parse::<RefinerPrecision>().unwrap().name(), name);
        }
        assert_eq!("bf16-unet".parse(), Ok(RefinerPrecision { unet: FloatDType::BF16, vae: FloatDType::F32 }));
        assert!("f64".parse::<RefinerPrecision>().unwrap_err().to_string().contains("bf16-unet"));
    }
}
